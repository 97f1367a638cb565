"""The cpu backend: kernel sources compiled by the host C++ compiler with OpenMP and loaded with ctypes."""

from __future__ import annotations

import ctypes
import functools
import os
import platform
import shlex
import shutil
import subprocess
import tempfile
import threading
import weakref
from pathlib import Path

import numpy as np

from .errors import KernelBuildError, KernelCacheError
from .signature import Signature, check_args, parse_kernels
from .sources import kernel_path, source_digest

# -fno-math-errno: kernels never read errno, and without it GCC will not vectorise a cell loop that calls
# sqrtf (measured 1.3-1.6x on the phase-field collide step); results are unchanged (IEEE sqrt either way)
HOST_FLAGS = ("-std=c++17", "-O3", "-march=native", "-fno-math-errno", "-fopenmp", "-shared", "-fPIC", "-x", "c++")

# the device-path host build (the cpu-device backend): the CUDA code paths (`#if CK_ON_GPU`) compiled by the
# host compiler, OpenMP loops where CUDA has threads (kernels/common.cuh); part of the flags, so of the cache key
DEVICE_PATH_DEFINE = "CK_DEVICE_PATH"

_CTYPES = {
    np.dtype(np.float32): ctypes.c_float,
    np.dtype(np.float64): ctypes.c_double,
    np.dtype(np.int32): ctypes.c_int32,
    np.dtype(np.uint32): ctypes.c_uint32,
    np.dtype(np.int64): ctypes.c_int64,
    np.dtype(np.uint8): ctypes.c_uint8,
    np.dtype(np.int8): ctypes.c_int8,
    np.dtype(np.uint16): ctypes.c_uint16,
}


def find_compiler() -> str | None:
    """The host C++ compiler: ``$CXX`` if set, else the first of g++, c++, clang++ on the PATH."""
    cxx = os.environ.get("CXX")
    if cxx:
        return shutil.which(cxx) or None
    for name in ("g++", "c++", "clang++"):
        path = shutil.which(name)
        if path:
            return path
    return None


def no_compiler_message() -> str:
    """Why :func:`find_compiler` found none, and the fix: a ``$CXX`` that is not an executable is named."""
    cxx = os.environ.get("CXX")
    if cxx:
        return f"CXX={cxx} is not an executable C++ compiler (set CXX to one, e.g. g++, or unset it)"
    return "no host C++ compiler found (set CXX or install g++)"


@functools.cache
def compiler_version(cxx: str) -> str:
    """First line of ``cxx --version``."""
    out = subprocess.run([cxx, "--version"], capture_output=True, text=True, check=False)
    return (out.stdout or out.stderr).splitlines()[0].strip() if (out.stdout or out.stderr) else "unknown"


@functools.cache
def _cpu_model() -> str:
    # -march=native: a library built on one CPU may not run on another, so the CPU is part of the cache key
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith(("model name", "flags")):
                return line
    except OSError:
        pass
    return platform.processor() or platform.machine()


def cache_dir() -> Path:
    """Where built kernel libraries are kept: ``$COUPLEKIT_CACHE_DIR``, else ``$XDG_CACHE_HOME/couplekit``."""
    env = os.environ.get("COUPLEKIT_CACHE_DIR")
    if env:
        return Path(env).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "couplekit" / "kernels"


def ensure_cache_dir() -> Path:
    """:func:`cache_dir`, made if missing; :class:`KernelCacheError` naming the fix when it is a file or cannot
    be made or written (the host backends check it when they are built, before a run allocates anything)."""
    out_dir = cache_dir()
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
        if not os.access(out_dir, os.W_OK | os.X_OK):
            raise PermissionError(f"{out_dir} is not writable")
    except OSError as exc:
        what = "is a file, not a folder" if out_dir.exists() and not out_dir.is_dir() else f"cannot be used ({exc})"
        raise KernelCacheError(
            f"the kernel cache {out_dir} {what}: set COUPLEKIT_CACHE_DIR to a writable folder (or unset it for "
            "$XDG_CACHE_HOME/couplekit/kernels)"
        ) from None
    return out_dir


def define_flags(defines: dict[str, int | float | str | bool] | None) -> list[str]:
    """``-D`` definitions in a stable order (the same for the host and the NVRTC path)."""
    flags = []
    for key in sorted(defines or {}):
        value = defines[key]
        if not key.isidentifier():
            raise ValueError(f"kernel define {key!r} is not a C identifier")
        if isinstance(value, bool):
            value = int(value)
        flags.append(f"-D{key}={value}")
    return flags


class HostBuild:
    """Outcome of one build: the library path and whether it came from the cache."""

    def __init__(self, library: Path, command: list[str], cached: bool):
        self.library = library
        self.command = command
        self.cached = cached


_build_lock = threading.Lock()


def build_library(
    source: Path, defines: dict | None = None, cxx: str | None = None, device_path: bool = False
) -> HostBuild:
    """Compile ``source`` into a shared library in the cache, or reuse the cached one.

    ``device_path``: build the CUDA code paths (``-DCK_DEVICE_PATH=1``, see kernels/common.cuh) instead of
    the host ones; a separate cache entry.

    The cache key hashes the source, every local header it includes, the flags, the compiler version and
    the CPU. Builds go to a temporary name in the cache directory and are renamed into place atomically,
    so concurrent processes never load a half-written library.
    """
    cxx = cxx or find_compiler()
    if cxx is None:
        raise KernelBuildError(no_compiler_message())
    if defines and DEVICE_PATH_DEFINE in defines:
        raise ValueError(f"{DEVICE_PATH_DEFINE} is set by device_path=True (the cpu-device backend), not a define")
    mode = [f"-D{DEVICE_PATH_DEFINE}=1"] if device_path else []
    flags = [*HOST_FLAGS, *mode, *define_flags(defines), f"-I{source.parent}"]
    key = source_digest(source, "\n".join([*flags, compiler_version(cxx), _cpu_model()]))
    out_dir = ensure_cache_dir()
    library = out_dir / f"{source.stem}{'-device' if device_path else ''}-{key[:20]}.so"
    command = [cxx, *flags, str(source), "-o", str(library)]
    if library.is_file():
        return HostBuild(library, command, cached=True)
    with _build_lock:
        fd, tmp = tempfile.mkstemp(prefix=f".{library.stem}-", suffix=".so.tmp", dir=out_dir)
        os.close(fd)
        try:
            cmd = [cxx, *flags, str(source), "-o", tmp]
            proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
            if proc.returncode != 0:
                raise KernelBuildError(
                    f"building {source.name} failed (exit {proc.returncode}).\n"
                    f"command: {shlex.join(cmd)}\n{proc.stderr.strip() or proc.stdout.strip()}"
                )
            os.replace(tmp, library)
        finally:
            if os.path.exists(tmp):
                os.unlink(tmp)
    return HostBuild(library, command, cached=False)


_POINTERS: dict[int, tuple[weakref.ref, int]] = {}


def _forget_pointer(key: int) -> None:
    _POINTERS.pop(key, None)


def data_pointer(a: np.ndarray) -> int:
    """``a.ctypes.data``, remembered per live array: building the ``ctypes`` view costs ~1.2 µs per array and a
    coupled step passes ~110 arrays to its kernels (0.13 ms of Fig. 13 small's ~3 ms step, 1 thread), while an
    array's data pointer is fixed for its lifetime.  Kept through a weak reference (the entry goes when the array
    does, so the cache keeps nothing alive and a reused id is not mistaken for the old array).  Only an in-place
    ``ndarray.resize`` could move the data of a live array; couplekit never resizes an array it passes to a kernel."""
    key = id(a)
    hit = _POINTERS.get(key)
    if hit is not None and hit[0]() is a:
        return hit[1]
    ptr = a.ctypes.data
    _POINTERS[key] = (weakref.ref(a, lambda _ref, key=key: _forget_pointer(key)), ptr)
    return ptr


class HostFunction:
    """A kernel of a host library, called as ``fn(n, *args)`` with NumPy arrays and scalars."""

    def __init__(self, cfunc, sig: Signature, set_threads=None):
        self._cfunc = cfunc
        self._set_threads = set_threads
        self.signature = sig
        cfunc.restype = None
        cfunc.argtypes = [ctypes.c_void_p if p.pointer else _CTYPES[p.dtype] for p in sig.params]

    def __call__(self, n: int, *args) -> None:
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 0:
            raise TypeError(f"{self.signature.name}: n must be a non-negative integer, got {n!r}")
        checked = check_args(self.signature, n, args, np.ndarray, "numpy.ndarray")
        cargs = [data_pointer(a) if isinstance(a, np.ndarray) else a for a in checked]
        if self._set_threads is not None:
            # the OpenMP thread count is process-wide state: set it per launch so that backends with
            # different thread counts in one process each get their own
            self._set_threads()
        self._cfunc(int(n), *cargs)  # ctypes releases the GIL for the call


class HostModule:
    """One kernel source compiled for the host with one set of defines; ``device_path=True`` builds its CUDA
    code paths (the cpu-device backend)."""

    def __init__(self, name: str, defines: dict | None = None, threads: int | None = None, device_path: bool = False):
        self.source = kernel_path(name)
        self.defines = dict(defines or {})
        self.device_path = bool(device_path)
        self.build = build_library(self.source, self.defines, device_path=self.device_path)
        self._lib = ctypes.CDLL(str(self.build.library))
        self.signatures = parse_kernels(self.source.read_text(), self.source.name, self.defines)
        self.threads = int(threads) if threads else None
        if self.threads:
            self._lib.couplekit_set_num_threads(ctypes.c_int(self.threads))
        self._functions: dict[str, HostFunction] = {}

    def function(self, name: str) -> HostFunction:
        """The kernel ``name``; a KeyError listing the available kernels if there is none."""
        if name not in self._functions:
            if name not in self.signatures:
                raise KeyError(f"{self.source.name} has no kernel {name!r} (has: {', '.join(self.signatures)})")
            set_threads = None
            if self.threads:
                setter, count = self._lib.couplekit_set_num_threads, ctypes.c_int(self.threads)
                set_threads = lambda: setter(count)  # noqa: E731
            self._functions[name] = HostFunction(getattr(self._lib, name), self.signatures[name], set_threads)
        return self._functions[name]

    def num_threads(self) -> int:
        """OpenMP threads the host kernels run on: this module's ``threads``, or OpenMP's current default. (The
        default is the process's: reading it for a module with its own count returned the count another module
        had set last, and the P2G sized its scratch and team from that.)"""
        return self.threads if self.threads else int(self._lib.couplekit_get_num_threads())
